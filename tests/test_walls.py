"""Verification of retaining walls, props and ground anchors (case/supports.py, physics/supports.py, the
excavation simulation) against limits, equilibrium and finite differences:

* an infinitely stiff prop holds its level after installation; a prop of vanishing stiffness is no prop;
  a preloaded prop or anchor carries its preload when it is locked;
* a wall of the ground's own stiffness is no wall (same mesh);
* a cantilever wall's bending moment from its stresses equals the moment of the forces the ground and
  the excavation put on it (the wall as a free body), and converges under refinement;
* every new value's sensitivity (E[wall], k and preload of props and anchors) and the ground's against
  central differences; one factorisation per configuration;
* bad walls, props, anchors and load cells refused, located.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data
from geoback.errors import CaseError
from geoback.physics.factory import make_simulation

pytestmark = pytest.mark.quick


@pytest.fixture(scope="module", autouse=True)
def geoback_cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("geoback-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GEOBACK_CACHE", str(folder))
        yield folder


def pit(props=True, anchors=False, wall=None, size=0.6, far=6.0, preload=0.0, k1=2e5, layers=None, stages=None,
        instruments=None):
    """A half-model pit 10 m wide (20 m between the walls), dug to 14 m in three lifts beside a 0.8 m wall
    to 24 m, two prop levels (or two anchors); soft clay over stiff clay."""
    if stages is None:
        stages = [{"name": "dig1", "excavate": ["L1"]}]
        if props or anchors:
            stages.append({"name": "level1", "install": ["P1"]})
        stages.append({"name": "dig2", "excavate": ["L2"]})
        if props or anchors:
            stages.append({"name": "level2", "install": ["P2"]})
        stages.append({"name": "dig3", "excavate": ["L3"]})
    d = {"name": "pit", "geometry": {"model": "half", "width": 60.0, "depth": 40.0, "openings": [
        {"name": "pit", "shape": "polygon", "boundary": [[0, 0], [10, 0], [10, -14], [0, -14]],
         "cuts": [[[0, -4], [10, -4]], [[0, -9], [10, -9]]],
         "parts": [{"name": "L1", "contains": [5, -2]}, {"name": "L2", "contains": [5, -6]},
                   {"name": "L3", "contains": [5, -12]}]}]},
        "ground": {"unit_weight": 19.0, "K0": 0.8, "layers": layers or [
            {"name": "soft", "top": 0.0, "E": 20000.0, "nu": 0.3}, {"name": "stiff", "top": 10.0, "E": 80000.0,
                                                                   "nu": 0.3}]},
        "mesh": {"size_tunnel": size, "size_far": far},
        "construction": {"walls": [wall or {"name": "W", "x": 10.4, "thickness": 0.8, "toe": 24.0, "E": 3e7,
                                            "nu": 0.2}],
                         "stages": stages},
        "instruments": instruments or [{"name": "I1", "kind": "inclinometer", "x": 10.4, "toe_depth": 24.0,
                                        "spacing": 1.0, "sigma": 1e-4, "readings": {stages[-1]["name"]: [0.0] * 24}},
                                       {"name": "S1", "kind": "points", "points": [[12, 0], [16, 0], [24, 0]],
                                        "components": ["uy"], "sigma": 1e-3,
                                        "readings": {stages[-1]["name"]: [0.0] * 3}}]}
    if props:
        d["construction"]["props"] = [
            {"name": "P1", "wall": "W", "depth": 1.5, "stiffness": k1, "preload": preload},
            {"name": "P2", "wall": "W", "depth": 7.0, "E": 2.1e8, "area": 0.01, "spacing": 4.0, "length": 20.0}]
    if anchors:
        d["construction"]["anchors"] = [
            {"name": "P1", "wall": "W", "depth": 2.0, "angle": 15, "free_length": 10.0, "fixed_length": 6.0,
             "stiffness": 3e4, "preload": preload},
            {"name": "P2", "wall": "W", "depth": 7.0, "angle": 20, "free_length": 8.0, "fixed_length": 6.0,
             "E": 1.95e8, "area": 4e-4, "spacing": 2.5, "preload": 150.0}]
    return d


def simulation(data, mesh=None):
    return make_simulation(LoadedCase(case_from_data(copy.deepcopy(data)), None, {}), mesh=mesh)


def last(sim, v):
    return sim.stage_displacements(v)[-1]


# ---------------------------------------------------------------------------- props: limits
def test_an_infinitely_stiff_prop_holds_its_level():
    stiff = simulation(pit(k1=1e12))
    free = simulation(pit(props=False))
    assert stiff.dofs == free.dofs  # the same mesh: supports do not enter it
    v, v0 = stiff.quantities(), free.quantities()
    C = stiff._C[0]
    k_in = list(stiff.stages).index("level1")
    U = stiff.stage_displacements(v)
    moved = abs(float((C @ (U[-1] - U[k_in])).item()))
    U0 = free.stage_displacements(v0)
    unpropped = abs(float((C @ (U0[-1] - U0[0])).item()))  # the same level after dig1, without props
    assert unpropped > 5e-3
    assert moved <= 1e-6 * unpropped
    force, _ = stiff.connector_force(v, "P1", len(stiff.stages) - 1)
    assert force > 100.0  # it carries the load that would have moved the level


def test_a_prop_of_vanishing_stiffness_is_no_prop():
    weak = pit()
    weak["construction"]["props"][0]["stiffness"] = 1e-6
    weak["construction"]["props"][1] = dict(weak["construction"]["props"][0], name="P2", depth=7.0)
    a = simulation(weak)
    b = simulation(pit(props=False))
    ua, ub = last(a, a.quantities()), last(b, b.quantities())
    assert np.abs(ua - ub).max() <= 1e-9 * np.abs(ub).max()


@pytest.mark.parametrize("kind", ["props", "anchors"])
def test_a_preloaded_support_carries_its_preload_when_locked(kind):
    sim = simulation(pit(props=kind == "props", anchors=kind == "anchors", preload=300.0))
    v = sim.quantities()
    k_in = list(sim.stages).index("level1")
    N, _ = sim.connector_force(v, "P1", k_in)
    assert abs(N - 300.0) <= 1e-9 * 300.0
    U = sim.stage_displacements(v)
    head = sim._C[0] @ (U[k_in] - U[k_in - 1])
    assert float(head[0]) < 0  # jacked: the prop lengthens / the anchor shortens, the wall pushed back
    N_end, _ = sim.connector_force(v, "P1", len(sim.stages) - 1)
    assert N_end > 300.0  # digging on loads it further


# ---------------------------------------------------------------------------- walls
def test_a_wall_of_the_grounds_own_stiffness_is_no_wall():
    one = [{"name": "clay", "top": 0.0, "E": 30000.0, "nu": 0.3}]
    walled = pit(props=False, layers=one, wall={"name": "W", "x": 10.4, "thickness": 0.8, "toe": 24.0, "E": 30000.0,
                                                "nu": 0.3})
    a = simulation(walled)
    bare = copy.deepcopy(walled)
    del bare["construction"]["walls"]
    b = simulation(bare, mesh=a.mesh)
    ua, ub = last(a, a.quantities()), last(b, b.quantities())
    assert np.abs(ua - ub).max() <= 1e-9 * np.abs(ub).max()
    stiff = simulation(pit(props=False, layers=one))
    head = np.array([[10.4, 0.0]])
    held = stiff.stage_displacements_at(stiff.quantities(), head, "dig3")[0, 0]
    soft = b.stage_displacements_at(b.quantities(), head, "dig3")[0, 0]
    assert soft < held < 0.0 and abs(held) < 0.95 * abs(soft)  # a concrete cantilever bends less: its top moves less


def test_a_wall_given_by_EA_and_EI_is_the_band_of_the_same_stiffness():
    t, E = 0.8, 3e7
    a = simulation(pit())
    b = simulation(pit(wall={"name": "W", "x": 10.4, "toe": 24.0, "EA": E * t, "EI": E * t ** 3 / 12, "nu": 0.2}))
    assert np.allclose(a.mesh.nodes, b.mesh.nodes)
    ua, ub = last(a, a.quantities()), last(b, b.quantities())
    assert np.abs(ua - ub).max() <= 1e-9 * np.abs(ua).max()


def _cantilever(size, layers=3):
    stages = [{"name": "dig1", "excavate": ["L1"]}, {"name": "dig2", "excavate": ["L2"]}]
    wall = {"name": "W", "x": 10.4, "thickness": 0.8, "toe": 24.0, "E": 3e7, "nu": 0.2, "layers": layers}
    return simulation(pit(props=False, size=size, far=10 * size, stages=stages, wall=wall))


def _free_body_moment(sim, v, depths):
    """Moment about the wall's section centre at each depth of the forces on the wall below it: the nodal
    forces its elements exert (internal force of their stress since installation), which at its boundary are
    what the ground and the released excavation put on it (and vanish inside it). The face edge a section
    crosses is split exactly: its traction is recovered from the face's nodal forces (the 1-D consistent
    mass system of the quadratic edges, M t = f) and integrated below the section only."""
    k = len(sim.stages) - 1
    st = sim._state(v)
    mat = sim._material(k)
    band = sim.plan.walls["W"]
    wall = np.flatnonzero(mat == 1 + list(sim.mesh.band_names).index("W"))
    u = sim.stage_displacements(v)[k]
    f = sim.fe.expand(sim._removal_load(wall, mat, st, u, {"W": np.zeros(sim.fe.nfree)})).reshape(-1, 2)
    X = sim.fe.nodes
    tri = sim.fe.tri[wall]
    nodes = np.unique(tri)
    inside = nodes[(X[nodes, 0] > band.faces[0] + 1e-6) & (X[nodes, 0] < band.faces[1] - 1e-6)
                   & (X[nodes, 1] < -band.top - 1e-6) & (X[nodes, 1] > -band.toe + 1e-6)]
    edges = [(t[a], t[m], t[b]) for t in tri for a, b, m in ((0, 1, 3), (1, 2, 4), (2, 0, 5))]
    faces = []
    for xf in band.faces:  # each face: its quadratic edges, sorted, and the traction on them
        on = [e for e in edges if abs(X[e[0], 0] - xf) < 1e-7 and abs(X[e[2], 0] - xf) < 1e-7]
        on = [e if X[e[0], 1] > X[e[2], 1] else e[::-1] for e in on]
        chain = sorted({n for e in on for n in e}, key=lambda n: -X[n, 1])
        at = {n: i for i, n in enumerate(chain)}
        M = np.zeros((len(chain), len(chain)))
        local = np.array([[4, 2, -1], [2, 16, 2], [-1, 2, 4]]) / 30.0
        for e in on:
            L = X[e[0], 1] - X[e[2], 1]
            idx = [at[e[0]], at[e[1]], at[e[2]]]
            M[np.ix_(idx, idx)] += L * local
        t = np.linalg.solve(M, f[chain])
        faces.append((xf, on, {n: t[i] for i, n in enumerate(chain)}))
    g, gw = np.polynomial.legendre.leggauss(6)
    out = []
    for z in depths:
        below = nodes[X[nodes, 1] < -z]
        Mz = -np.sum((X[below, 0] - band.x) * f[below, 1] - (X[below, 1] + z) * f[below, 0])
        for xf, on, t in faces:
            for e in on:
                ya, yb = X[e[0], 1], X[e[2], 1]  # ya above yb
                if not (yb < -z < ya):
                    continue
                L = ya - yb
                te = np.array([t[n] for n in e])  # (3, 2) traction at the edge's nodes (top, mid, bottom)

                def shape(s):  # s from 0 (top) to 1 (bottom)
                    return np.array([(1 - s) * (1 - 2 * s), 4 * s * (1 - s), s * (2 * s - 1)])

                for j, n in enumerate(e):  # take out this edge's share of the nodes counted below
                    if X[n, 1] < -z:
                        share = sum(w * shape((q + 1) / 2)[j] * (shape((q + 1) / 2) @ te) for q, w in zip(g, gw)) * L / 2
                        Mz += (X[n, 0] - band.x) * share[1] - (X[n, 1] + z) * share[0]
                s0 = (ya + z) / L  # the section's place on the edge; integrate the traction below it
                for q, w in zip(g, gw):
                    s = s0 + (1 - s0) * (q + 1) / 2
                    y = ya - s * L
                    tr = shape(s) @ te
                    Mz -= w * (1 - s0) * L / 2 * ((xf - band.x) * tr[1] - (y + z) * tr[0])
        out.append(Mz)
    return np.array(out), np.abs(f[inside]).max(), np.abs(f[nodes]).max()


def test_cantilever_moment_from_the_walls_stresses_equals_the_moment_of_the_earth_pressures():
    """Within 0.5 % of the largest moment at every depth, on two meshes."""
    for size in (0.6, 0.3):
        sim = _cantilever(size)
        v = sim.quantities()
        wf = sim.wall_forces(v)["W"]
        M = wf.M[-1]
        depths = np.array([2.0, 4.5, 6.0, wf.depths[int(np.argmax(np.abs(M)))], 12.0, 18.0, 22.0])
        Mn, interior, boundary = _free_body_moment(sim, v, depths)
        assert interior <= 1e-9 * boundary  # no force inside the wall: equilibrium of its elements
        gap = np.abs(np.interp(depths, wf.depths, M) - Mn) / np.abs(M).max()
        print(size, np.round(gap * 100, 3), "% of the largest moment", np.abs(M).max())
        assert gap.max() <= 5e-3, (size, gap)


def test_wall_top_deflection_and_largest_moment_converge_under_refinement():
    """The whole mesh halved twice (the ground's sizes and the wall's elements through its thickness)."""
    tops, moments = [], []
    for size, layers in ((1.0, 2), (0.5, 4), (0.25, 8)):
        sim = _cantilever(size, layers)
        wf = sim.wall_forces(sim.quantities())["W"]
        tops.append(wf.ux[-1][0])
        moments.append(np.abs(wf.M[-1]).max())
    d1, d2 = abs(tops[1] - tops[0]), abs(tops[2] - tops[1])
    print(f"wall top deflection {tops} m, observed order {np.log2(d1 / d2):.2f}")
    assert d2 < d1 and d2 <= 1e-3 * abs(tops[2])
    # the largest moment is converged to its sampling noise (0.1 m along the wall) on the coarsest mesh already
    spread = (max(moments) - min(moments)) / moments[-1]
    print(f"largest moment {moments} kNm/m, spread {100 * spread:.2f} %")
    assert spread <= 5e-3


# ---------------------------------------------------------------------------- sensitivities
def _richardson(sim, v, name):
    def central(h):
        vp, vm = dict(v), dict(v)
        vp[name] += h
        vm[name] -= h
        return (sim.predict(vp).x - sim.predict(vm).x) / (2 * h)
    h = 1e-2 * abs(v[name]) if v[name] else 10.0
    return (4 * central(h / 2) - central(h)) / 3


@pytest.mark.parametrize("kind", ["props", "anchors"])
def test_every_sensitivity_against_central_differences(kind):
    ins = [{"name": "I1", "kind": "inclinometer", "x": 10.4, "toe_depth": 24.0, "spacing": 2.0, "sigma": 1e-4,
            "readings": {"level2": [0.0] * 12, "dig3": [0.0] * 12}},
           {"name": "C1", "kind": "load_cell", "support": "P1", "sigma": 5.0, "readings": {"level2": [0.0],
                                                                                          "dig3": [0.0]}},
           {"name": "C2", "kind": "load_cell", "support": "P2", "sigma": 5.0, "readings": {"dig3": [0.0]}}]
    sim = simulation(pit(props=kind == "props", anchors=kind == "anchors", preload=100.0, instruments=ins))
    v = sim.quantities()
    names = ["E[W]", "nu[W]", "k[P1]", "preload[P1]", "k[P2]", "preload[P2]", "E[soft]", "E[stiff]", "K0"]
    A = sim.predict(v, names, sensitivities=True).A
    for j, name in enumerate(names):
        fd = _richardson(sim, v, name)
        scale = np.abs(A[:, j]).max()
        assert scale > 0, name
        assert np.abs(fd - A[:, j]).max() <= 1e-6 * scale, name


def test_one_factorisation_per_configuration():
    """Five stages: dig1, the first level's preload (on the dig1 configuration: reused), dig2 with the
    first level acting, the second level's preload (reused), dig3 with both: three configurations."""
    sim = simulation(pit(preload=100.0))
    v = dict(sim.quantities())
    sim.predict(v)
    before = sim.counters.factorisations
    v["k[P1]"] *= 1.5
    sim.predict(v)
    assert sim.counters.factorisations - before == 2  # dig2, dig3 carry k[P1]; dig1's stays
    v["E[soft]"] *= 1.1
    sim.predict(v, ["E[soft]", "k[P1]"], sensitivities=True)
    assert sim.counters.factorisations - before == 5


# ---------------------------------------------------------------------------- bad input
def _error(data):
    try:
        case_from_data(copy.deepcopy(data))
    except CaseError as exc:
        return str(exc)
    return ""


def test_bad_walls_props_and_anchors_are_refused_located():
    d = pit()
    d["construction"]["walls"][0]["toe"] = 12.0
    assert "construction.walls[0].toe" in _error(d) and "below the final dig" in _error(d)
    d = pit()
    d["construction"]["props"][1]["depth"] = 12.0
    e = _error(d)
    assert "construction.props[1].depth" in e and "not yet excavated" in e
    d = pit()
    d["construction"]["props"][0]["wall"] = "W2"
    e = _error(d)
    assert "construction.props[0].wall" in e and "'W2'" in e
    d = pit()
    d["construction"]["stages"].insert(0, {"name": "cast", "install": ["W"]})
    d["construction"]["stages"][0:2] = [d["construction"]["stages"][1], d["construction"]["stages"][0]]
    e = _error(d)
    assert "construction.walls[0]" in e and "before the ground beside it" in e
    d = pit(props=False, anchors=True)
    d["construction"]["anchors"][0].update(free_length=60.0)
    e = _error(d)
    assert "construction.anchors[0]" in e and "leaving the model" in e
    d = pit()
    d["construction"]["props"][0]["stiffness"] = 0
    e = _error(d)
    assert "construction.props[0].stiffness" in e and "greater than 0" in e
    d = pit()
    d["construction"]["props"][0]["preload"] = "500 kN"
    e = _error(d)
    assert "construction.props[0].preload" in e and "kN/m" in e
    d = pit()
    d["construction"]["props"][0]["preload"] = "0.5 MN/m"
    assert _error(d) == ""
    d = pit()
    d["construction"]["props"][0].pop("stiffness")
    e = _error(d)
    assert "construction.props[0]" in e and "E, area and spacing" in e
    d = pit()
    d["instruments"].append({"name": "C9", "kind": "load_cell", "support": "P7", "sigma": 5.0,
                             "readings": {"dig3": [1.0]}})
    e = _error(d)
    assert "instruments[2].support" in e and "'P7'" in e
    d = pit()
    d["construction"]["walls"][0]["E"] = None
    e = _error(d)
    assert "construction.walls[0]" in e and "thickness and E, or by EA and EI" in e


def test_a_strut_between_two_walls_of_a_full_model_is_the_half_models_prop_to_the_symmetry_plane():
    """The symmetric pit modelled whole, the struts from wall to wall (`to`), against the half-model whose
    struts are springs to the symmetry plane with half their length: the same wall movement and strut force
    (to the difference of the two gmsh meshes)."""
    half = pit(props=True)
    half["construction"]["props"][0]["stiffness"] = None
    half["construction"]["props"][0].update(E=2.1e8, area=0.02, spacing=6.0, length=20.0)
    full = copy.deepcopy(half)
    full["geometry"].update(model="full", width=120.0)
    full["geometry"]["openings"][0].update(boundary=[[-10, 0], [10, 0], [10, -14], [-10, -14]],
                                           cuts=[[[-10, -4], [10, -4]], [[-10, -9], [10, -9]]])
    full["construction"]["walls"].append(dict(full["construction"]["walls"][0], name="W2", x=-10.4))
    for p in full["construction"]["props"]:
        p.update(to="W2", length=None)
    a, b = simulation(half), simulation(full)
    assert b.connectors["P2"].spring_length == pytest.approx(20.0) and a.connectors["P2"].spring_length == 10.0
    assert a.connectors["P2"].stiffness == pytest.approx(2 * b.connectors["P2"].stiffness)  # shortened twice
    va, vb = a.quantities(), b.quantities()
    head = np.array([[10.4, 0.0], [10.4, -7.0], [10.4, -14.0]])
    ua = a.stage_displacements_at(va, head, "dig3")
    ub = b.stage_displacements_at(vb, head, "dig3")
    mirror = b.stage_displacements_at(vb, head * [-1, 1], "dig3")
    assert np.abs(ub[:, 0] + mirror[:, 0]).max() <= 1e-3 * np.abs(ub[:, 0]).max()  # symmetric
    assert np.abs(ua - ub).max() <= 0.02 * np.abs(ua).max()
    for name in ("P1", "P2"):
        Na, Nb = a.connector_force(va, name, 4)[0], b.connector_force(vb, name, 4)[0]
        assert Nb == pytest.approx(Na, rel=0.02), name
