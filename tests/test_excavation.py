"""Verification of openings excavated by element removal (geoback.physics.excavation, case/layout.py,
case/sequence.py, physics/section_mesh.py) against the traction-release model, closed forms and
finite differences:

* a circular opening removed element by element equals today's traction release on the same ground
  (the meshes outside the opening are the same: gmsh meshes the same boundary), and its surface
  settlement converges under refinement (observed order printed);
* staged removal without supports equals removal at once (linear ground), heading + bench + invert too;
* a whole-width strip excavated from a 1-D column heaves by the closed-form oedometric amount;
* the load of what is removed is its weight, and the supports' reactions balance it;
* Kirsch (a deep opening, element removal);
* every sensitivity against central differences (Richardson-extrapolated);
* twin tunnels far apart superpose two single-tunnel half-models; close together the second trough
  leans towards the first;
* bad sections and sequences refused, located, before meshing.
"""
from __future__ import annotations

import copy
import re
import math

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


def simulation(data):
    return make_simulation(LoadedCase(case_from_data(copy.deepcopy(data)), None, {}))


SURFACE = [[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [7.0, 0.0], [12.0, 0.0]]


def points(pts=SURFACE, stage=None, components=("ux", "uy")):
    ins = {"name": "S1", "kind": "points", "points": pts, "components": list(components), "sigma": 0.001,
           "readings": [0.0] * (len(pts) * len(components))}
    if stage:
        ins["stage"] = stage
    return [ins]


def ground(E=40000.0, nu=0.3, K0=0.7, gamma=20.0, layers=None):
    return {"unit_weight": gamma, "K0": K0, "layers": layers or [{"name": "clay", "top": 0.0, "E": E, "nu": nu}]}


def circle_section(size=0.3, far=4.0, model="half", width=60.0, depth=45.0, instruments=None, **kw):
    return {"name": "circle", "geometry": {"model": model, "width": width, "depth": depth, "openings": [
        {"name": "tunnel", "shape": "circle", "centre": [0.0, -15.0], "radius": 3.0}]},
        "ground": ground(**kw), "mesh": {"size_tunnel": size, "size_far": far},
        "instruments": instruments or points()}


def circle_legacy(size=0.3, far=4.0, width=60.0, depth=45.0, instruments=None, **kw):
    return {"name": "legacy", "geometry": {"radius": 3.0, "axis_depth": 15.0, "width": width, "depth": depth},
            "ground": ground(**kw), "mesh": {"size_tunnel": size, "size_far": far},
            "instruments": instruments or points()}


# ---------------------------------------------------------------------------- against traction release
def test_element_removal_equals_traction_release_on_the_same_ground():
    removal = simulation(circle_section())
    release = simulation(circle_legacy())
    assert type(removal).__name__ == "ExcavationSimulation" and type(release).__name__ == "ElasticSimulation"
    v = removal.quantities()
    x1 = removal.predict(v).x
    x2 = release.predict(release.quantities()).x
    assert np.abs(x1).max() > 1e-3  # millimetres of settlement: a real comparison
    assert np.abs(x1 - x2).max() <= 1e-9 * np.abs(x2).max()


def test_element_removal_converges_under_refinement():
    """The crown's settlement on meshes h, h/2, h/4, h/8 (the wall's element size and the far size
    halved together): both models agree at every level, and the changes shrink at least twofold per
    halving (observed order >= 1; printed)."""
    values = []
    crown = points([[0.0, -12.0]], components=("uy",))
    for size, far in ((1.2, 12.0), (0.6, 6.0), (0.3, 3.0), (0.15, 1.5)):
        sim = simulation(circle_section(size=size, far=far, instruments=crown))
        leg = simulation(circle_legacy(size=size, far=far, instruments=crown))
        x = sim.predict(sim.quantities()).x[0]
        assert x == pytest.approx(leg.predict(leg.quantities()).x[0], rel=1e-4)  # (the floor: 0.5 %)
        values.append(x)
    d = np.abs(np.diff(values))
    orders = np.log2(d[:-1] / d[1:])
    print(f"crown settlement: {[f'{1e3 * v:.5f} mm' for v in values]}, observed orders {np.round(orders, 2)}")
    assert np.all(orders >= 1.0)
    assert d[-1] <= 2e-4 * abs(values[-1])


# ---------------------------------------------------------------------------- staging
def natm(stages=None, linings=None, instruments=None, cuts=(-15.5, -18.0)):
    parts = [{"name": "heading", "contains": [0.0, -12.0]}, {"name": "bench", "contains": [0.0, -17.0]},
             {"name": "invert", "contains": [0.0, -18.8]}][:len(cuts) + 1]
    data = {"name": "natm", "geometry": {"model": "half", "width": 50.0, "depth": 40.0, "openings": [
        {"name": "tunnel", "shape": "horseshoe", "centre": [0.0, -15.0], "crown_radius": 5.0, "side_radius": 8.0,
         "height": 9.5, "invert_radius": 12.0,
         "cuts": [[[-6.0, y], [6.0, y]] for y in cuts], "parts": parts}]},
        "ground": ground(layers=[{"name": "fill", "top": 0.0, "E": 20000.0, "nu": 0.3, "unit_weight": 18.0},
                                 {"name": "clay", "top": 5.0, "E": 60000.0, "nu": 0.3}]),
        "mesh": {"size_tunnel": 0.5, "size_far": 5.0},
        "instruments": instruments or points(SURFACE + [[0.0, -8.0], [8.0, -15.0]])}
    if stages:
        data["construction"] = {"stages": stages}
        if linings:
            data["construction"]["linings"] = linings
    return data


def test_staged_removal_without_supports_equals_removal_at_once():
    at_once = simulation(natm())
    staged = simulation(natm(stages=[{"name": "heading", "excavate": ["heading"]},
                                     {"name": "bench", "excavate": ["bench"]},
                                     {"name": "invert", "excavate": ["invert"]}]))
    x1 = at_once.predict(at_once.quantities()).x
    x2 = staged.predict(staged.quantities()).x
    assert np.abs(x1).max() > 1e-3
    assert np.abs(x1 - x2).max() <= 1e-9 * np.abs(x1).max()
    # a partial release of the heading continued later ends at the same place
    partial = simulation(natm(stages=[{"name": "heading", "excavate": ["heading"], "release": 0.4},
                                      {"name": "rest", "excavate": ["bench", "invert"]},
                                      {"name": "heading-rest", "release": 1.0}]))
    x3 = partial.predict(partial.quantities()).x
    assert np.abs(x1 - x3).max() <= 1e-9 * np.abs(x1).max()


def test_oedometric_heave_of_a_whole_width_strip():
    """A strip 6 m deep over the whole width of a half-model (ux fixed at both sides, bottom fixed):
    the column below unloads by gamma h, its top heaves by gamma h (H - h) / M, M the constrained
    modulus (two layers: the sum of each layer's share)."""
    h, H, W = 6.0, 30.0, 10.0
    layers = [{"name": "sand", "top": 0.0, "E": 30000.0, "nu": 0.25, "unit_weight": 19.0},
              {"name": "clay", "top": 12.0, "E": 15000.0, "nu": 0.35, "unit_weight": 21.0}]
    data = {"name": "heave", "geometry": {"model": "half", "width": W, "depth": H, "openings": [
        {"name": "pit", "shape": "polygon", "boundary": [[0.0, 0.0], [W, 0.0], [W, -h], [0.0, -h]]}]},
        "ground": {"unit_weight": 20.0, "K0": 0.6, "layers": layers},
        "mesh": {"size_tunnel": 1.0, "size_far": 2.0},
        "instruments": points([[2.0, -h], [5.0, -h], [5.0, -20.0]], components=("uy",))}
    sim = simulation(data)
    x = sim.predict(sim.quantities()).x

    def M(E, nu):
        return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))

    load = 19.0 * h
    top = load * ((12.0 - h) / M(30000.0, 0.25) + (H - 12.0) / M(15000.0, 0.35))
    at20 = load * (H - 20.0) / M(15000.0, 0.35)
    assert x[0] == pytest.approx(top, rel=1e-3) and x[1] == pytest.approx(top, rel=1e-3)
    assert x[2] == pytest.approx(at20, rel=1e-3)


def test_the_load_of_what_is_removed_is_its_weight_and_the_supports_balance_it():
    from shapely.geometry import Point

    sim = simulation(circle_section(model="full", width=80.0))
    v = sim.quantities()
    fe = sim.fe
    u = sim.stage_displacements(v)[-1]
    # the internal force of the ground that remains, at every dof (supports included)
    active = np.flatnonzero(sim.mesh.part < 0)
    exx, eyy, gxy, w, _, _ = fe.element_quadrature(active)
    from geoback.physics.ground import plane_strain_isotropic

    d11, d22, d12, d33 = plane_strain_isotropic(v["E[clay]"], v["nu[clay]"])
    ue = fe.expand(u)[fe.edofs[active]]
    ex, ey, gx = (np.einsum("eaq,ea->eq", op, ue) for op in (exx, eyy, gxy))
    sxx, syy, sxy = d11 * ex + d12 * ey, d12 * ex + d22 * ey, d33 * gx
    f_int = np.einsum("eaq,eq->ea", exx, sxx * w) + np.einsum("eaq,eq->ea", eyy, syy * w) + \
        np.einsum("eaq,eq->ea", gxy, sxy * w)
    internal = np.zeros(fe.ndof)
    np.add.at(internal, fe.edofs[active].ravel(), f_int.ravel())
    reactions = internal[fe.fixed]
    weight = 20.0 * Point(0.0, -15.0).buffer(3.0, 2048).area
    fixed_y = np.flatnonzero(fe.fixed) % 2 == 1
    fixed_x = ~fixed_y
    # the ground that remains is pushed up by the weight that was removed: the supports hold it down
    removed = fe.element_quadrature(np.flatnonzero(sim.mesh.part >= 0))[3].sum()  # the removed elements' area
    assert -reactions[fixed_y].sum() == pytest.approx(20.0 * removed, rel=1e-8)
    assert -reactions[fixed_y].sum() == pytest.approx(weight, rel=1e-5)  # (the mesh's circle against the true one)
    assert abs(reactions[fixed_x].sum()) <= 1e-8 * weight


def test_kirsch_deep_opening_by_element_removal():
    """A deep opening (R = 1 m at 400 m) in a full model: the wall's radial displacement against
    Kirsch with p0 = gamma x depth (the stress varies by 0.25 % across the opening)."""
    R, L, E, nu, K0, gamma = 1.0, 400.0, 1000.0, 0.25, 0.5, 1.0
    data = {"name": "kirsch", "geometry": {"model": "full", "width": 2 * L, "depth": 2 * L, "openings": [
        {"name": "hole", "shape": "circle", "centre": [0.0, -L], "radius": R}]},
        "ground": ground(E=E, nu=nu, K0=K0, gamma=gamma), "mesh": {"size_tunnel": R / 12, "size_far": L / 10},
        "instruments": points([[0.0, -L + R], [R, -L], [-R, -L]], components=("ux", "uy"))}
    sim = simulation(data)
    x = sim.predict(sim.quantities()).x.reshape(-1, 2)
    G = E / (2 * (1 + nu))
    p0 = gamma * L

    def ur(theta):
        return -p0 * R / (4 * G) * ((1 + K0) - (1 - K0) * (3 - 4 * nu) * np.cos(2 * theta))

    assert x[0, 1] == pytest.approx(ur(np.pi / 2), rel=0.015)  # crown, radial = +y
    assert x[1, 0] == pytest.approx(ur(0.0), rel=0.015)  # right springline, radial = +x
    assert -x[2, 0] == pytest.approx(ur(0.0), rel=0.015)  # left springline, radial = -x


# ---------------------------------------------------------------------------- sensitivities
LINED = dict(stages=[{"name": "heading", "excavate": ["heading"], "release": 0.4},
                     {"name": "heading-lined", "install": ["shotcrete", "temporary"]},
                     {"name": "bench", "excavate": ["bench", "invert"], "remove": ["temporary"], "release": 0.6},
                     {"name": "closed", "install": ["ring"]}],
             linings=[{"name": "shotcrete", "on": "heading", "thickness": 0.25, "E": "10 GPa", "nu": 0.2},
                      {"name": "temporary", "on": "heading", "side": "cut", "thickness": 0.3, "E": "8 GPa", "nu": 0.2},
                      {"name": "ring", "on": "bench", "thickness": 0.25, "E": "12 GPa", "nu": 0.2}])


@pytest.fixture(scope="module")
def lined():
    instruments = points(SURFACE + [[0.0, -8.0], [8.0, -15.0], [-6.0, -20.0]], stage=None)
    ins = [dict(instruments[0], readings={s: [0.0] * 16 for s in ("heading", "heading-lined", "bench", "closed")})]
    wall = -3.0 + math.sqrt(64.0 - 0.5 ** 2)  # the side wall (radius 8 about (-3, -15)) 0.5 m below the springline
    ins.append({"name": "C1", "kind": "convergence", "points": [[-wall, -15.5], [wall, -15.5]], "sigma": 0.001,
                "readings": {"heading": [0.0], "heading-lined": [0.0]}})
    return simulation(natm(instruments=ins, **LINED))


def _richardson(sim, v, name, rel=1e-2):
    def central(h):
        vp, vm = dict(v), dict(v)
        vp[name] += h
        vm[name] -= h
        return (sim.predict(vp).x - sim.predict(vm).x) / (2 * h)
    h = rel * abs(v[name])
    return (4 * central(h / 2) - central(h)) / 3


def test_every_sensitivity_against_central_differences(lined):
    sim = lined
    v = sim.quantities()
    names = sorted(v)
    assert {"beta[heading]", "beta[bench]", "E[shotcrete]", "nu[temporary]", "E[ring]", "gamma", "gamma[fill]",
            "K0", "E[clay]", "nu[fill]"} <= set(names)
    A = sim.predict(v, names, sensitivities=True).A
    for j, name in enumerate(names):
        fd = _richardson(sim, v, name)
        scale = np.abs(A[:, j]).max()
        assert scale > 0, name
        assert np.abs(fd - A[:, j]).max() <= 1e-6 * scale, name


def test_configurations_are_factorised_once(lined):
    """A new run at other moduli factorises each configuration that releases load once (four stages,
    four configurations); the same values again cost nothing."""
    sim = lined
    v = dict(sim.quantities())
    v["E[clay]"] *= 1.1
    before = sim.counters.factorisations
    sim.predict(v)
    assert sim.counters.factorisations - before == 4
    sim.predict(v)
    assert sim.counters.factorisations - before == 4


def test_linings_carry_load_and_the_temporary_invert_releases_its_own(lined):
    sim = lined
    v = sim.quantities()
    stiff = dict(v)
    soft = dict(v, **{"E[shotcrete]": 1e3, "E[temporary]": 1e3, "E[ring]": 1e3})
    u_stiff, u_soft = sim.stage_displacements(stiff), sim.stage_displacements(soft)
    crown = sim.survey.labels.index(next(lab for lab in sim.survey.labels if lab.stage == "closed" and lab.x == 0.0
                                         and lab.y == -8.0 and lab.component == "uy"))
    x_stiff, x_soft = sim.predict(stiff).x[crown], sim.predict(soft).x[crown]
    assert x_soft < x_stiff < 0  # a stiff lining holds the ground up
    stress = sim.element_stress(v, k=1)
    band = sim.mesh.band == sim.mesh.band_names.index("shotcrete")
    assert np.all(np.isfinite(stress[band]))  # installed
    assert np.nanmean(stress[band][:, 0] + stress[band][:, 1]) < 0  # in compression
    assert np.all(np.isnan(sim.element_stress(v, k=2)[sim.mesh.band == sim.mesh.band_names.index("temporary")]))


# ---------------------------------------------------------------------------- twin tunnels
def twin(a, stages=True, width=240.0):
    data = {"name": "twin", "geometry": {"model": "full", "width": width, "depth": 50.0, "openings": [
        {"name": "west", "shape": "circle", "centre": [-a, -15.0], "radius": 3.0},
        {"name": "east", "shape": "circle", "centre": [a, -15.0], "radius": 3.0}]},
        "ground": ground(), "mesh": {"size_tunnel": 0.4, "size_far": 6.0},
        "instruments": points([[x, 0.0] for x in np.linspace(-30.0, 30.0, 13)], components=("uy",))}
    if stages:
        data["construction"] = {"stages": [{"name": "west", "excavate": ["west"]}, {"name": "east", "excavate": ["east"]}]}
    return data


def test_twin_tunnels_far_apart_superpose_two_single_tunnels():
    a = 30.0
    sim = simulation(twin(a))
    trough = sim.predict(sim.quantities()).x
    single = circle_section(width=120.0, depth=50.0, size=0.4, far=6.0,
                            instruments=points([[abs(x - a), 0.0] for x in np.linspace(-30.0, 30.0, 13)]
                                               + [[abs(x + a), 0.0] for x in np.linspace(-30.0, 30.0, 13)],
                                               components=("uy",)))
    half = simulation(single)
    s = half.predict(half.quantities()).x
    superposed = s[:13] + s[13:]
    assert np.abs(trough - superposed).max() <= 0.01 * np.abs(superposed).max()


def test_the_second_trough_of_close_tunnels_leans_towards_the_first():
    a = 5.0
    sim = simulation(twin(a, width=160.0))
    x = np.linspace(-30.0, 30.0, 13)
    u = sim.stage_displacements(sim.quantities())
    Iy = sim.fe.interpolation(np.column_stack([x, np.zeros_like(x)]))[1]
    first, both = Iy @ u[0], Iy @ u[1]
    second = both - first
    assert np.argmin(first) == 5  # above the west tunnel (x = -5)
    east = 7  # x = 5
    towards, away = second[east - 2], second[east + 2]  # 10 m towards the first tunnel, 10 m away from it
    assert towards < away < 0  # the second trough settles more on the first tunnel's side: asymmetric
    assert abs(towards - away) > 0.05 * abs(second[east])
    # both dug, the section is symmetric again (to the mesh's asymmetry)
    assert np.abs(both - both[::-1]).max() <= 0.02 * np.abs(both).max()


# ---------------------------------------------------------------------------- bad input
def _problems(data) -> str:
    with pytest.raises(CaseError) as info:
        case_from_data(data)
    return " | ".join(str(p) for p in (info.value.problems or [info.value]))


@pytest.mark.parametrize("change, expected", [
    (lambda d: d["geometry"]["openings"].append({"name": "other", "shape": "circle", "centre": [2.0, -15.0],
                                                 "radius": 3.0}), "overlapping"),
    (lambda d: d["geometry"]["openings"][0].update(centre=[0.0, -2.0]), "inside the ground"),
    (lambda d: d["geometry"]["openings"][0].update(centre=[20.0, -15.0], radius=45.0), "inside"),
    (lambda d: d["geometry"]["openings"][0].update(cuts=[[[-9.0, -30.0], [9.0, -30.0]]],
                                                   parts=[{"name": "a", "contains": [0.0, -15.0]}]), "missing the opening"),
    (lambda d: d["geometry"]["openings"][0].update(cuts=[[[-9.0, -15.0], [9.0, -15.0]]],
                                                   parts=[{"name": "a", "contains": [0.0, -14.0]}]), "tile"),
    (lambda d: d["geometry"]["openings"][0].update(cuts=[[[-9.0, -15.0], [9.0, -15.0]]],
                                                   parts=[{"name": "a", "contains": [0.0, -14.0]},
                                                          {"name": "b", "contains": [1.0, -13.0]},
                                                          {"name": "c", "contains": [0.0, -16.0]}]), "same piece"),
    (lambda d: d["geometry"]["openings"].__setitem__(0, {"name": "tunnel", "shape": "polygon", "boundary": [
        [-3.0, -12.0], [2.0, -12.0], [3.0, -18.0]]}), "symmetric"),
])
def test_bad_sections_are_refused_located(change, expected):
    data = circle_section()
    change(data)
    text = _problems(data)
    assert "geometry.openings" in text and expected in text


@pytest.mark.parametrize("stages, linings, expected", [
    ([{"name": "a", "excavate": ["heading"]}, {"name": "b", "excavate": ["heading", "bench", "invert"]}], None,
     "excavated again"),
    ([{"name": "a", "install": ["shotcrete"]}, {"name": "b", "excavate": ["tunnel"]}],
     [{"name": "shotcrete", "on": "heading", "thickness": 0.25, "E": "10 GPa", "nu": 0.2}], "not yet excavated"),
    ([{"name": "a", "release": 0.5}, {"name": "b", "excavate": ["tunnel"]}], None, "excavates nothing"),
    ([{"name": "a", "excavate": ["nowhere"]}], None, "expected the name of an opening or part"),
    ([{"name": "a", "excavate": ["tunnel"], "release": 0.6}, {"name": "b", "release": 0.3}], None, "do not decrease"),
    ([{"name": "a", "excavate": ["tunnel"]}], [{"name": "t", "on": "tunnel", "side": "cut", "thickness": 0.2,
                                                "E": "10 GPa", "nu": 0.2}], "part for a lining along cut lines"),
])
def test_bad_sequences_are_refused_located(stages, linings, expected):
    text = _problems(natm(stages=stages, linings=linings))
    assert "construction" in text and expected in text


def test_a_reading_of_excavated_ground_is_refused_located():
    data = natm(stages=[{"name": "heading", "excavate": ["heading"]}, {"name": "bench", "excavate": ["bench", "invert"]}],
                instruments=[{"name": "X", "kind": "points", "points": [[0.0, -17.0]], "components": ["uy"],
                              "sigma": 0.001, "readings": {"heading": [0.0], "bench": [0.0]}}])
    with pytest.raises(CaseError, match=r"instruments\[0\].*excavated by stage 'bench'"):
        simulation(data)
    data["instruments"][0]["readings"] = {"heading": [0.0]}  # read before the bench is dug: the ground is there
    from geoback.inference.identification import prepare

    data["parameters"] = [{"name": "E[clay]", "initial": 50000.0}]
    analysis = prepare(LoadedCase(case_from_data(data), None, {}))
    sim = analysis.simulation
    assert sim.survey.labels[0].stage == "heading"
    assert np.isfinite(sim.predict(sim.quantities()).x).all()


def test_mirrored_readings_in_a_half_model(capsys):
    """Points at x < 0 in a half-model read their mirror images: u_y the same, u_x with its sign changed."""
    sim = simulation(circle_section(instruments=points([[-4.0, 0.0], [4.0, 0.0], [-5.0, -15.0], [5.0, -15.0]])))
    x = sim.predict(sim.quantities()).x.reshape(-1, 2)
    assert "mirror images" in capsys.readouterr().err
    assert x[0, 1] == pytest.approx(x[1, 1], rel=1e-12) and x[0, 0] == pytest.approx(-x[1, 0], rel=1e-12)
    assert x[2, 0] == pytest.approx(-x[3, 0], rel=1e-12) and x[3, 0] < 0  # the wall moves in


@pytest.mark.parametrize("lined_section", [False, True])
def test_every_part_and_band_is_meshed_with_its_area(lined_section):
    """The mesh's parts and lining bands cover the layout's polygons (a part the cut lines leave whole, or
    an OpenCASCADE boolean returning nothing, would otherwise vanish into the ground)."""
    from geoback.case import layout as lay

    data = natm(**LINED) if lined_section else natm()
    case = case_from_data(data)
    sim = simulation(data)
    mesh, fe = sim.mesh, sim.fe
    area = fe.element_quadrature(np.arange(fe.ne))[3].sum(axis=1)
    regions = lay.regions(case.geometry)
    for k, name in enumerate(mesh.part_names):
        half = regions[name][1].intersection(lay.ground_polygon(case.geometry)).area
        assert area[mesh.part == k].sum() == pytest.approx(half, rel=2e-3), name
    if lined_section:
        from geoback.case.sequence import Sequence

        for k, (name, ln) in enumerate(Sequence.of(case).linings.items()):
            band = lay.lining_band(case.geometry, ln).intersection(lay.ground_polygon(case.geometry)).area
            assert mesh.band_names[k] == name
            assert area[mesh.band == k].sum() == pytest.approx(band, rel=0.05), name


def test_validate_refuses_a_bad_sequence_with_file_line_and_exit_2(tmp_path):
    """The command line: `geoback validate` on a section whose lining is installed before its part is
    dug says where (file:line:column: field), what was expected and found, exit 2, no traceback."""
    import subprocess
    import sys

    import yaml

    data = natm(stages=[{"name": "a", "install": ["shotcrete"]}, {"name": "b", "excavate": ["tunnel"]}],
                linings=[{"name": "shotcrete", "on": "heading", "thickness": 0.25, "E": "10 GPa", "nu": 0.2}])
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "validate", str(path)], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert re.search(r"bad\.yaml:\d+:\d+: construction\.stages\[0\]\.install\[0\]: expected lining 'shotcrete' "
                     r"installed at or after the excavation of 'heading', found 'heading' not yet excavated",
                     out.stderr + out.stdout)
