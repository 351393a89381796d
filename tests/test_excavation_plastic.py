"""Verification of staged excavation by element removal in yielding (Mohr-Coulomb) ground
(geoback.physics.excavation_plastic) against the linear-elastic removal model, today's traction-release
model, the closed form and finite differences, on real gmsh meshes with the real incremental solver:

* c' -> infinity is the linear-elastic ExcavationSimulation (heading, lining, temporary invert removed,
  bench, ring): readings and sensitivities within 1e-8 relative (measured 1.4e-11 and 8.5e-10);
* a circular opening removed in one excavation stage (released in two fractions) is today's
  PlasticSimulation (traction release) on the same ground mesh: readings within 1e-12, sensitivities
  within 1e-9 (measured 1.0e-14 and 7e-13);
* Salencon: a deep circular opening removed element by element (R = 1 m at 400 m, K0 = 1, p0 = gamma
  x depth = 1000 kPa) against the closed form at 90 % and full release, within the 2 % of today's
  tests (measured: plastic radius 0.05-0.19 %, wall displacement 0.04-0.21 %);
* every sensitivity (E, nu, K0, gamma, c, phi, psi, beta per stage; the linings' E, nu) against
  central differences of the replayed schedule between runs on the same branch (no point changing
  between elastic and plastic), within 1e-6 of the column's largest entry (measured: heading and bench
  in four stages 1.2e-11 to 7.9e-9; with linings, slow, 1.1e-10 to 3.0e-7, E[ring] the largest);
* heading then bench in yielding ground: the plastic zone grows from stage to stage and is reported
  (plastic_zone, the field's plastic[stage] cells), excavated ground left out of it;
* a lining installed in the stage that excavates its part: the part's ground stress (the band's
  included) is released and the lining starts stress-free, so a lining of negligible stiffness is
  no lining (elastic and yielding);
* failures in words: a dilation angle above the friction angle, an in-situ stress beyond the
  strength, a Newton iteration that does not converge (naming the construction stage).
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data
from geoback.errors import CaseError, ForwardFailure
from geoback.physics.excavation import ExcavationSimulation
from geoback.physics.excavation_plastic import YieldingExcavationSimulation
from geoback.physics.factory import make_simulation
from geoback.physics.plasticity import DeepTunnelMC
from geoback.physics.plastic import PROBE_TOL

@pytest.fixture(scope="module", autouse=True)
def geoback_cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("geoback-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GEOBACK_CACHE", str(folder))
        yield folder


def simulation(data, mesh=None):
    return make_simulation(LoadedCase(case_from_data(copy.deepcopy(data)), None, {}), mesh=mesh)


def marl(**change):
    layer = {"name": "marl", "top": 0.0, "E": 40000.0, "nu": 0.3, "model": "mohr-coulomb", "c": 50.0, "phi": 30.0,
             "psi": 5.0}
    layer.update(change)
    return {k: v for k, v in layer.items() if v is not None}


ELASTIC = dict(model=None, c=None, phi=None, psi=None)  # marl(**ELASTIC): the same layer, linear elastic


def points(pts, components=("ux", "uy"), name="S1"):
    return {"name": name, "kind": "points", "points": pts, "components": list(components), "sigma": 0.001,
            "readings": [0.0] * (len(pts) * len(components))}


def heading_bench(stages, linings=None, layer=None, size=0.6, K0=0.9, axis=15.0):
    """A horseshoe (8 m wide, the springline `axis` deep) cut into a heading, a bench and an invert,
    in a half-model."""
    y = -axis
    data = {"name": "heading-bench", "geometry": {"model": "half", "width": 40.0, "depth": axis + 20.0, "openings": [
        {"name": "tunnel", "shape": "horseshoe", "centre": [0.0, y], "crown_radius": 4.0, "side_radius": 6.0,
         "height": 7.5, "invert_radius": 10.0, "cuts": [[[-5.0, y - 0.5], [5.0, y - 0.5]], [[-5.0, y - 2.5], [5.0, y - 2.5]]],
         "parts": [{"name": "heading", "contains": [0.0, y + 2.0]}, {"name": "bench", "contains": [0.0, y - 1.5]},
                   {"name": "invert", "contains": [0.0, y - 3.2]}]}]},
        "ground": {"unit_weight": 20.0, "K0": K0, "layers": [layer or marl()]},
        "mesh": {"size_tunnel": size, "size_far": 6.0},
        "instruments": [points([[0.0, 0.0], [3.0, 0.0], [8.0, 0.0], [0.0, y + 6.0], [6.0, y + 1.0], [5.0, y - 5.0]]),
                        {"name": "C1", "kind": "convergence", "points": [[0.0, y + 4.0], [4.0, y]], "sigma": 0.0005,
                         "readings": [0.0]}],
        "construction": {"stages": stages}}
    if linings:
        data["construction"]["linings"] = linings
    return data


STAGED = [{"name": "heading", "excavate": ["heading"], "release": 0.5},
          {"name": "heading-past", "release": 1.0},
          {"name": "bench", "excavate": ["bench", "invert"], "release": 0.7},
          {"name": "closed", "release": 1.0}]
LINED = [{"name": "heading", "excavate": ["heading"], "release": 0.4},
         {"name": "heading-lined", "install": ["shotcrete", "temporary"]},
         {"name": "bench", "excavate": ["bench", "invert"], "remove": ["temporary"], "release": 0.6},
         {"name": "closed", "install": ["ring"]}]
LININGS = [{"name": "shotcrete", "on": "heading", "thickness": 0.25, "E": "10 GPa", "nu": 0.2},
           {"name": "temporary", "on": "heading", "side": "cut", "thickness": 0.3, "E": "8 GPa", "nu": 0.2},
           {"name": "ring", "on": "bench", "thickness": 0.25, "E": "12 GPa", "nu": 0.2}]


# ---------------------------------------------------------------------------- the registry and names
@pytest.mark.quick
def test_chosen_for_openings_in_mohr_coulomb_ground_and_names():
    sim = simulation(heading_bench(STAGED))
    assert isinstance(sim, YieldingExcavationSimulation) and sim.stages == [s["name"] for s in STAGED]
    q = sim.quantities()
    assert {"E[marl]", "nu[marl]", "K0", "gamma", "c[marl]", "phi[marl]", "psi[marl]", "beta[heading]",
            "beta[heading-past]", "beta[bench]", "beta[closed]"} == set(q)
    assert sim.canonical("c") == "c[marl]" and sim.canonical("gamma") == "gamma" and sim.canonical("n") is None
    assert sim.unit("phi[marl]") == "deg" and sim.unit("gamma") == "kN/m3" and sim.unit("beta[bench]") == "-"
    assert sim.limits("psi[marl]", q).hi == 30.0 and sim.piecewise_smooth
    # the same case with linear-elastic ground is the elastic removal model
    assert type(simulation(heading_bench(STAGED, layer=marl(**ELASTIC)))) is ExcavationSimulation
    # every part of the opening cut twice is meshed as its own (the heading lies wholly on one side of the
    # second cut: it was once meshed as ground that no stage removed)
    from geoback.case.layout import regions

    area = sim.ops.w.sum(axis=1)
    for k, name in enumerate(sim.mesh.part_names):
        half = regions(sim.loaded.case.geometry)[name][1].area / 2  # (a half-model)
        assert area[sim.mesh.part == k].sum() == pytest.approx(half, rel=1e-3), name


# ---------------------------------------------------------------------------- against the elastic removal model
@pytest.mark.quick
def test_huge_cohesion_is_the_elastic_removal_model():
    """c' = 1e9 kPa: no point yields, and the readings of every stage (a lined heading, its temporary
    invert removed with the bench, the ring closed) are those of ExcavationSimulation on the same mesh."""
    sim = simulation(heading_bench(LINED, LININGS))
    elastic = simulation(heading_bench(LINED, LININGS, layer=marl(**ELASTIC)), mesh=sim.mesh)
    assert type(elastic) is ExcavationSimulation
    values = dict(sim.quantities(), **{"c[marl]": 1e9})
    x = sim.predict(values).x
    assert not sim.solution(values).yielded.any()
    for k in range(len(LINED)):
        np.testing.assert_allclose(sim.stage_displacements(values)[k], elastic.stage_displacements(elastic.quantities())[k],
                                   rtol=0, atol=1e-8 * np.abs(elastic.stage_displacements(elastic.quantities())[k]).max())
    names = sorted(elastic.quantities())  # the ground's, the unit weight, the releases, the linings' E and nu
    assert {"gamma", "beta[bench]", "E[temporary]", "nu[ring]"} <= set(names)
    exact = elastic.predict(elastic.quantities(), names, sensitivities=True)
    x_el = exact.x
    assert np.abs(x_el).max() > 1e-3
    assert np.abs(x - x_el).max() <= 1e-8 * np.abs(x_el).max()
    # and the sensitivities: the DDM through elastic points, linings included, is the linear recursion's
    A = sim.predict(values, names, sensitivities=True).A
    for j, name in enumerate(names):
        assert np.abs(A[:, j] - exact.A[:, j]).max() <= 1e-8 * np.abs(exact.A[:, j]).max(), name
    # the stress of the ground that is there: sigma_0 + D B u of the elastic run, at every point
    run, U = sim.solution(values), elastic.stage_displacements(elastic.quantities())
    lam, G = 40000.0 * 0.3 / (1.3 * 0.4), 40000.0 / 2.6
    sigma0 = sim._inputs(values).sigma0
    for k in (1, len(LINED) - 1):
        ground = np.repeat(sim._material(k) == 0, sim.ops.nq)
        e = sim.ops.strain(U[k])
        expected = sigma0 + np.stack([lam * (e[:, 0] + e[:, 1]) + 2 * G * e[:, 0], lam * (e[:, 0] + e[:, 1])
                                      + 2 * G * e[:, 1], lam * (e[:, 0] + e[:, 1]), G * e[:, 2]], axis=1)
        assert np.abs(run.sigma[k][ground] - expected[ground]).max() <= 1e-8 * np.abs(expected[ground]).max()
    # a lining's stress from its installation on (compressed), none where excavated
    s = sim.element_stress(values, k=1)
    band = sim.mesh.band == sim.mesh.band_names.index("shotcrete")
    assert np.all(np.isfinite(s[band])) and np.mean(s[band][:, 0] + s[band][:, 1]) < 0
    np.testing.assert_array_equal(np.isfinite(s[:, 0]), np.isfinite(elastic.element_stress(elastic.quantities(), k=1)[:, 0]))
    # its plastic-zone figure: every stage elastic in words, the linings standing after the last stage drawn
    from geoback.reports.plots.plastic import plastic_zone_figure

    zone = sim.plastic_zone(values)
    fig = plastic_zone_figure(zone, name="lined", case=sim.loaded.case)
    assert fig._suptitle.get_text().split("\n")[0] == ("lined: plastic zone around the tunnel at the case's values - "
                                                        "the ground stays elastic")
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert [t for t in legend if "stays elastic" in t] == [f"after '{st['name']}'" + (
        f" (release {st['release']:.2g})" if st.get("release", 1.0) < 1 else "") + ": the ground stays elastic"
        for st in LINED]
    standing = next(t for t in legend if "standing after" in t)
    assert "'ring'" in standing and standing.endswith(f"standing after '{LINED[-1]['name']}'")
    assert len(fig.axes) == 1  # no colour bar without plastic strain
    fig.clear()


# ---------------------------------------------------------------------------- against traction release
def circle(section: bool):
    ground = {"unit_weight": 20.0, "K0": 0.9, "layers": [marl()]}
    ins = [points([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [7.0, 0.0], [12.0, 0.0], [0.0, -11.5], [3.5, -15.0],
                   [6.0, -20.0]])]
    mesh = {"size_tunnel": 0.4, "size_far": 6.0}
    if section:
        return {"name": "circle", "geometry": {"model": "half", "width": 40.0, "depth": 40.0, "openings": [
            {"name": "tunnel", "shape": "circle", "centre": [0.0, -15.0], "radius": 3.0}]}, "ground": ground,
            "mesh": mesh, "instruments": ins, "construction": {"stages": [
                {"name": "near", "excavate": ["tunnel"], "release": 0.7}, {"name": "final", "release": 1.0}]}}
    return {"name": "legacy", "geometry": {"radius": 3.0, "axis_depth": 15.0, "width": 40.0, "depth": 40.0},
            "ground": ground, "mesh": mesh, "instruments": ins,
            "construction": {"stages": [{"name": "near", "release": 0.7}, {"name": "final", "release": 1.0}]}}


@pytest.mark.quick
def test_one_removal_stage_is_the_traction_release_model():
    """The opening removed in one stage (released to 0.7, then to 1) and today's PlasticSimulation
    (wall traction released to 0.7, then 1) on the same ground: gmsh meshes the same boundary, the
    removal load equals the traction release, the schedules are the same, so the runs are the same
    to rounding (measured 2.5e-14), sensitivities included; yielding at both stages."""
    removal, release = simulation(circle(True)), simulation(circle(False))
    assert type(release).__name__ == "PlasticSimulation"
    v1, v2 = removal.quantities(), release.quantities()
    names = ["E[marl]", "nu[marl]", "K0", "c[marl]", "phi[marl]", "psi[marl]", "beta[near]", "beta[final]"]
    assert set(v2) <= set(v1) and set(names) <= set(v2)
    p1, p2 = removal.predict(v1, names, sensitivities=True), release.predict(v2, names, sensitivities=True)
    assert np.abs(p2.x).max() > 1e-3
    assert np.abs(p1.x - p2.x).max() <= 1e-12 * np.abs(p2.x).max()
    for j, name in enumerate(names):
        assert np.abs(p1.A[:, j] - p2.A[:, j]).max() <= 1e-9 * np.abs(p2.A[:, j]).max(), name
    run, ref = removal.solution(v1), release.solution(v2).result
    assert run.schedule == ref.schedule
    assert 0 < run.yielded[0].sum() < run.yielded[1].sum()
    assert list(run.yielded.sum(axis=1)) == list(ref.yielded.reshape(2, -1).sum(axis=1))


# ---------------------------------------------------------------------------- Salencon
P0, R, L = 1000.0, 1.0, 400.0


@pytest.mark.quick
@pytest.mark.parametrize("psi", [0.0, 10.0, 30.0])
def test_deep_opening_by_element_removal_against_salencon(psi):
    """Element removal of a deep circular opening (half-model, wall elements R/10 growing by 0.2, 8.4 k
    DOFs), K0 = 1 under gravity with gamma L = p0 = 1000 kPa at the axis (the stress varies by 0.44 %
    across the plastic zone), E = 100 MPa, nu = 0.4, c = 110 kPa, phi = 30 deg; released to 0.9, then 1:
    the plastic radius (where the radial stress reaches the critical pressure, ``deep_tunnel.measure``'s
    way) and the mean radial wall displacement against the closed form, within today's 2 %."""
    E, nu, c, phi = 1.0e5, 0.4, 110.0, 30.0
    data = {"name": "salencon", "geometry": {"model": "half", "width": L, "depth": 2 * L, "openings": [
        {"name": "hole", "shape": "circle", "centre": [0.0, -L], "radius": R}]},
        "ground": {"unit_weight": P0 / L, "K0": 1.0, "layers": [
            {"name": "rock", "top": 0.0, "E": E, "nu": nu, "model": "mohr-coulomb", "c": c, "phi": phi, "psi": psi}]},
        "mesh": {"size_tunnel": R / 10, "size_far": L / 10, "growth": 0.2},
        "construction": {"stages": [{"name": "near", "excavate": ["hole"], "release": 0.9},
                                    {"name": "full", "release": 1.0}]},
        "instruments": [points([[R, -L]], components=("ux",))]}
    sim = simulation(data)
    run = sim.solution(sim.quantities())
    fe, ops = sim.fe, sim.ops
    d = ops.point_coordinates() - np.array([0.0, -L])
    r = np.hypot(d[:, 0], d[:, 1])
    cx, sy = d[:, 0] / r, d[:, 1] / r
    dn = fe.nodes - np.array([0.0, -L])
    wall = np.flatnonzero(np.abs(np.hypot(dn[:, 0], dn[:, 1]) - R) < 1e-6 * R)
    assert len(wall) > 40
    ground = np.repeat(sim.mesh.part < 0, ops.nq)
    for k, lam in enumerate((0.9, 1.0)):
        cf = DeepTunnelMC.released(P0, R, E, nu, c, np.radians(phi), np.radians(psi), lam)
        assert cf.plastic and cf.out_of_plane_is_intermediate()
        s = run.sigma[k]
        srr = s[:, 0] * cx ** 2 + s[:, 1] * sy ** 2 + 2 * s[:, 3] * cx * sy
        assert not run.yielded[k][~ground].any()  # the excavated ground is not part of the zone
        outer = r[run.plastic[k]].max()
        band = (np.abs(r - outer) <= 0.15 * outer) & ground
        roots = np.roots(np.polyfit(r[band] - outer, srr[band] + cf.critical_pressure, 3))
        roots = roots[np.abs(roots.imag) < 1e-12].real
        rp = outer + roots[np.argmin(np.abs(roots))]
        u = fe.expand(run.u[k]).reshape(-1, 2)[wall]
        ur = ((u[:, 0] * dn[wall, 0] + u[:, 1] * dn[wall, 1]) / R).mean()
        print(f"psi {psi:g}, lambda {lam:g}: R_p {rp:.4f} (closed form {cf.plastic_radius:.4f}, "
              f"{rp / cf.plastic_radius - 1:+.2e}), wall {ur:.5e} ({cf.wall_displacement:.5e}, "
              f"{ur / cf.wall_displacement - 1:+.2e})")
        assert rp == pytest.approx(cf.plastic_radius, rel=0.02)
        assert ur == pytest.approx(cf.wall_displacement, rel=0.02)
        assert abs(outer - cf.plastic_radius) <= 0.15 * cf.plastic_radius
        assert not run.yielded[k][r > 1.2 * cf.plastic_radius].any()


# ---------------------------------------------------------------------------- sensitivities
def _same_branch_difference(fd, values, name, steps, richardson):
    """Central differences of the replayed simulation `fd` at the first relative step of `steps` whose
    perturbed runs stay on the branch of the run at `values` (the same points yielding in the same
    increments: ``_Run.branch``), Richardson-extrapolated from h and 2h if asked; (column, step), or
    (None, None) when every step crosses a kink."""
    base = fd.solution(values).branch
    for rel in steps:
        h = rel * abs(values[name])
        x, branches = {}, []
        for k in ((-2, -1, 1, 2) if richardson else (-1, 1)):
            x[k] = fd.predict({**values, name: values[name] + k * h}).x
            branches.append(fd.solution({**values, name: values[name] + k * h}).branch)
        if all(b == base for b in branches):
            d1 = (x[1] - x[-1]) / (2 * h)
            return ((4 * d1 - (x[2] - x[-2]) / (4 * h)) / 3 if richardson else d1), rel
    return None, None


def _check_sensitivities(sim, names, steps, richardson=False, tol=1e-6):
    """DDM columns against finite differences of the replayed schedule (no halving, Newton tolerance
    REPLAY_TOL) on the base run's branch: a quadrature point that changes between elastic and plastic
    inside the interval puts a kink in it (at a step of 1e-5 measured 4.7e-5 for beta[heading-past] of the
    heading-bench case, against 2e-10 at 1e-6 where no point changes). Returns {name: (difference, step)}."""
    values = sim.quantities()
    A = sim.predict(values, names, sensitivities=True).A
    fd = sim.replaying(values)
    found = {}
    for j, name in enumerate(names):
        tried = steps(name) if callable(steps) else steps
        col, step = _same_branch_difference(fd, values, name, tried, richardson)
        assert col is not None, f"{name}: every step {tried} crosses a kink"
        scale = np.abs(A[:, j]).max()
        assert scale > 0, name
        found[name] = (float(np.abs(col - A[:, j]).max() / scale), step)
    print({k: f"{d:.1e} (step {h:g})" for k, (d, h) in found.items()})
    assert all(np.isfinite(d) for d, _ in found.values()), found  # (a value at 0 has no relative step)
    assert max(d for d, _ in found.values()) <= tol, found
    return found


@pytest.mark.quick
def test_every_sensitivity_against_central_differences():
    """Heading released in two stages, then bench and invert in two: every value of the case, the
    history of the heading's plastic zone carried into the bench's removal load (eqn R3)."""
    sim = simulation(heading_bench(STAGED))
    run = sim.solution(sim.quantities())
    assert run.yielded[1].sum() > run.yielded[0].sum() > 0 and run.yielded[3].sum() > run.yielded[1].sum()
    _check_sensitivities(sim, sorted(sim.quantities()), steps=(1e-5, 1e-6))


SUPPORTED = [{"name": "heading", "excavate": ["heading"], "release": 0.4},
             {"name": "heading-lined", "install": ["shotcrete", "temporary"]},
             {"name": "bench", "excavate": ["bench", "invert"], "remove": ["temporary"], "install": ["ring"],
              "release": 0.5},
             {"name": "closed", "release": 1.0}]
YOUNG = [dict(LININGS[0], E="5 GPa"), dict(LININGS[1], E="4 GPa"), dict(LININGS[2], E="6 GPa")]


@pytest.mark.slow
def test_every_sensitivity_with_linings_against_central_differences():
    """Shotcrete and a temporary invert in the heading; the invert removed with the bench (its stress
    released) and the ring installed with it, carrying half the bench's load: the linings' E and nu too
    (young shotcrete, so that they move the readings measurably: a lining that barely deforms has a column
    at the rounding floor of the Newton iteration, e.g. 2e-6 m for E[ring] of 12 GPa installed last)."""
    sim = simulation(heading_bench(SUPPORTED, YOUNG))
    names = sorted(sim.quantities())
    assert {"E[shotcrete]", "nu[temporary]", "E[ring]", "beta[heading]", "beta[bench]"} <= set(names)
    assert sim.solution(sim.quantities()).yielded[-1].any()
    # the linings' values move the readings little (a stiff lining barely deforms): their columns need larger
    # steps than the rounding floor of the Newton iteration allows at 1e-5 (measured for nu[ring]: 3e-6 at 1e-3),
    # and Richardson's extrapolation there (an elastic lining's values rarely change which ground points yield)
    linings = {f"{q}[{ln['name']}]" for ln in YOUNG for q in ("E", "nu")}
    _check_sensitivities(sim, names, steps=lambda n: (1e-2, 1e-3, 1e-4) if n in linings else (1e-4, 1e-5, 1e-6),
                         richardson=True)


# ---------------------------------------------------------------------------- staged removal and the plastic zone
@pytest.mark.quick
def test_heading_then_bench_grows_a_plastic_zone_that_is_reported():
    sim = simulation(heading_bench(STAGED))
    values = sim.quantities()
    zone = sim.plastic_zone(values)
    assert [s.stage for s in zone.stages] == sim.stages
    areas = [s.area for s in zone.stages]
    assert 0 < areas[0] < areas[1] < areas[3] and areas[2] <= areas[3]
    assert all(s.yielded_points > 0 for s in zone.stages)
    assert zone.stages[1].max_radius > zone.radius  # beyond the opening's equivalent radius
    assert [s.release for s in zone.stages] == [0.5, 1.0, 0.7, 1.0]
    f = sim.field(values)
    for k, stage in enumerate(sim.stages):
        cells = f.cell_data[f"plastic[{stage}]"]
        assert cells.shape == (len(sim.mesh.triangles),) and cells.max() > 0
        gone = sim._material(k) < 0  # excavated by the stage: not in its zone
        assert not cells[gone].any() and not f.cell_data[f"plastic_strain[{stage}]"][gone].any()
    assert np.all(np.isnan(f.cell_data["stress_xx"][sim.mesh.part >= 0]))
    assert np.all(np.isfinite(f.cell_data["stress_xx"][sim.mesh.part < 0]))
    # readings: the crown settles more once the heading yields than elastic ground would let it
    elastic = simulation(heading_bench(STAGED, layer=marl(**ELASTIC)), mesh=sim.mesh)
    crown = 2 * 3 + 1  # the point 2 m above the crown, uy
    assert sim.predict(values).x[crown] < 1.2 * elastic.predict(elastic.quantities()).x[crown] < 0


@pytest.mark.quick
def test_the_plastic_zone_figure_draws_the_openings_as_they_stand():
    """The figure of a heading and bench: the case named in its title, the horseshoe's outline and cut
    line drawn (not a circle of its equivalent radius, no crown or invert named on it), the ground
    excavated by the last stage left out, every stage's zone in the legend in depths and areas, and the
    frame holding every point that yielded."""
    from matplotlib.collections import PolyCollection

    from geoback.reports.plots.plastic import plastic_zone_figure
    from geoback.reports.section import stage_state

    sim = simulation(heading_bench(STAGED))
    case = sim.loaded.case
    zone = sim.plastic_zone(sim.quantities())
    assert zone.about == "the centroid of opening 'tunnel'"
    assert "from the centroid of opening 'tunnel'" in " ".join(zone.lines())
    fig = plastic_zone_figure(zone, name="hb", case=case)
    ax = fig.axes[0]
    head, strength = fig._suptitle.get_text().split("\n")
    assert head == "hb: plastic zone around the tunnel at the case's values"
    assert strength == "('marl': c' = 50 kPa, phi' = 30 deg, psi = 5 deg)"  # the strength it was drawn at (marl())
    assert not {"crown", "springline", "invert"} & {t.get_text() for t in ax.texts}
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    for s in zone.stages:
        assert any(t.startswith(f"plastic zone after '{s.stage}'") and f"{s.bottom_depth:.1f} m deep" in t
                   for t in legend), (s.stage, legend)
    assert "openings' walls before excavation" in legend
    void, lining = stage_state(case, sim.mesh)
    assert void.any()
    coloured = next(c for c in ax.collections if isinstance(c, PolyCollection) and c.get_array() is not None)
    assert len(coloured.get_paths()) == int((~void & (lining < 0)).sum())  # the standing ground alone
    dashed = [ln for ln in ax.lines if ln.get_linestyle() == "--" and len(ln.get_xdata()) > 10]
    outline = np.column_stack([dashed[0].get_xdata(), dashed[0].get_ydata()])
    r = np.hypot(*(outline[np.isfinite(outline[:, 0])] - zone.centre).T)
    assert r.max() / r.min() > 1.2  # the horseshoe's outline, not a circle about its centroid
    yielded = sim.mesh.nodes[np.unique(sim.mesh.triangles[np.any(zone.cell_yielded > 0, axis=0), :3])]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 <= yielded[:, 0].min() and yielded[:, 0].max() <= x1
    assert y0 <= yielded[:, 1].min() and yielded[:, 1].max() <= y1


@pytest.mark.quick
def test_a_run_near_the_last_starts_from_it_carried_by_its_sensitivities():
    """Issue 22: a run at values near the last run with sensitivities starts each increment from that run
    carried to first order (u + du/dp dp), not from its solution as it was: the same readings (to the
    Newton tolerance) for fewer factorisations, on every stage of a heading and bench that yields.
    (Readings-only runs, as probes: a fit's trial point would also compute its sensitivities. A probe's
    Newton tolerance is plastic.PROBE_TOL.)"""
    sim = simulation(heading_bench(STAGED))
    values = sim.quantities()
    names = ["E[marl]", "K0", "c[marl]", "phi[marl]"]
    near = {**values, "E[marl]": 1.01 * values["E[marl]"], "c[marl]": 0.99 * values["c[marl]"],
            "phi[marl]": values["phi[marl]"] + 0.1}

    def readings(s, at):
        before = s.counters.factorisations
        with s.probing():
            x = s.predict(at).x
        return x, s.counters.factorisations - before

    sim.predict(values, names, sensitivities=True)
    x_carried, carried = readings(sim, near)
    plain = simulation(heading_bench(STAGED), mesh=sim.mesh)  # the last run without sensitivities
    readings(plain, values)
    x_plain, as_it_was = readings(plain, near)
    cold = simulation(heading_bench(STAGED), mesh=sim.mesh)
    x_cold, from_scratch = readings(cold, near)
    scale = np.abs(x_cold).max()
    assert np.abs(x_carried - x_cold).max() <= 10 * PROBE_TOL * scale
    assert np.abs(x_plain - x_cold).max() <= 10 * PROBE_TOL * scale
    assert carried < as_it_was < from_scratch, (carried, as_it_was, from_scratch)  # measured: 40, 49, 75


@pytest.mark.quick
@pytest.mark.parametrize("yielding", [False, True])
def test_a_lining_installed_where_its_part_is_excavated_starts_stress_free(yielding):
    """A lining installed in the stage that excavates its part replaces ground that is removed: that
    ground's stress is released with the rest of the part and the lining starts stress-free, so a
    lining of negligible stiffness (1e-3 kPa) is no lining at all (the same mesh, bands as ground)."""
    layer = marl() if yielding else marl(**ELASTIC)
    stages = [{"name": "heading", "excavate": ["heading"], "install": ["shotcrete"], "release": 0.6},
              {"name": "heading-past", "release": 1.0},
              {"name": "bench", "excavate": ["bench", "invert"], "install": ["ring"]}]
    lined = simulation(heading_bench(stages, [LININGS[0], LININGS[2]], layer=layer))
    bare = simulation(heading_bench([{"name": "heading", "excavate": ["heading"], "release": 0.6},
                                     {"name": "heading-past", "release": 1.0},
                                     {"name": "bench", "excavate": ["bench", "invert"]}], layer=layer),
                      mesh=lined.mesh)
    soft = dict(lined.quantities(), **{"E[shotcrete]": 1e-3, "E[ring]": 1e-3})
    x, x0 = lined.predict(soft).x, bare.predict(bare.quantities()).x
    assert np.abs(x0).max() > 1e-3
    assert np.abs(x - x0).max() <= 1e-6 * np.abs(x0).max()


# ---------------------------------------------------------------------------- failures in words
@pytest.mark.quick
def test_failures_are_said_in_words():
    sim = simulation(heading_bench(STAGED[:2]))
    values = sim.quantities()
    with pytest.raises(ForwardFailure, match=r"psi\[marl\] = 35 deg above the friction angle"):
        sim.predict(dict(values, **{"psi[marl]": 35.0}))
    with pytest.raises(ForwardFailure, match="in-situ stress exceeds the Mohr-Coulomb strength"):
        sim.predict(dict(values, **{"K0": 4.0, "c[marl]": 1.0}))
    stuck = copy.copy(sim)
    stuck.options = replace(sim.options, max_iterations=1, refine=False)
    stuck.release()
    with pytest.raises(ForwardFailure, match=r"construction stage 'heading' \(1 of 2\).*Newton"):
        stuck.predict(values)
    # a mohr-coulomb layer with openings validates; linear triangles are refused, located
    data = heading_bench(STAGED)
    data["mesh"]["order"] = 1
    with pytest.raises(CaseError, match=r"mesh.order.*quadratic"):
        case_from_data(data)
