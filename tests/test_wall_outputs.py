"""What an engineer sees of retaining walls, props and anchors (worth/walls.py, reports/walls.py,
reports/plots/walls.py, the support and wall forecasts, field.vtu), against the simulation itself:

* walls.csv and supports.csv hold, number by number, ``wall_forces`` and ``connector_force``;
* their stds are the first-order propagation of C_p: exact for the supports (against central
  differences of the force), central differences for the walls (against another step);
* the forecast kinds 'support' and 'wall' equal direct evaluation, their sensitivities central
  differences, their units kN per prop or kN/m per metre run; a load cell's forecast is an axial force
  in kN;
* bad support and wall forecasts are refused, located (exit 2 through the CLI);
* the wall and support figures, the mesh figure and field.vtu show the wall (the shipped case end to
  end: test_wall_run.py, slow).
"""
from __future__ import annotations

import copy
import csv
import subprocess
import sys

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data
from geoback.physics.factory import make_simulation
from test_walls import _error  # the case's first refusal, in words

from test_walls import pit

pytestmark = pytest.mark.quick
NAMES = ["E[soft]", "K0", "k[P1]"]
C = np.diag([2000.0, 0.03, 1e4]) ** 2  # a covariance of the three (kPa, -, kN/m/m)


@pytest.fixture(scope="module", autouse=True)
def geoback_cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("geoback-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GEOBACK_CACHE", str(folder))
        yield folder


def case_data(forecasts=()):
    d = pit(size=1.0, far=8.0)
    d["forecasts"] = list(forecasts)
    return d


@pytest.fixture(scope="module")
def model():
    data = case_data([{"name": "p2", "kind": "support", "support": "P2", "stage": "dig3"},
                      {"name": "p1", "kind": "support", "support": "P1"},
                      {"name": "w", "kind": "wall", "wall": "W", "quantities": ["M", "V"], "stage": "dig3"}])
    loaded = LoadedCase(case_from_data(copy.deepcopy(data)), None, {})
    sim = make_simulation(loaded)
    return loaded, sim, sim.quantities()


def std_of(F):
    return np.sqrt(np.einsum("ij,jk,ik->i", F, C, F))


@pytest.fixture(scope="module")
def results(model):
    from geoback.worth.walls import walls_and_supports

    loaded, sim, v = model
    return walls_and_supports(sim, loaded.case, v, NAMES, std_of)


def _central(f, v, names, rel=1e-4):
    cols = []
    for n in names:
        h = rel * max(abs(v[n]), 1e-3)
        up, down = dict(v), dict(v)
        up[n], down[n] = v[n] + h, v[n] - h
        cols.append((np.asarray(f(up), float) - np.asarray(f(down), float)) / (2 * h))
    return np.stack(cols, axis=-1)


# ---------------------------------------------------------------------------- walls.csv, supports.csv
def test_walls_and_supports_csv_hold_the_simulations_numbers(model, results, tmp_path):
    from geoback.reports.walls import write_walls

    loaded, sim, v = model
    write_walls(results, tmp_path)
    wf = sim.wall_forces(v)["W"]
    rows = list(csv.DictReader(open(tmp_path / "walls.csv")))
    stages = list(sim.stages)
    assert {r["stage"] for r in rows} == set(stages)  # the wall stands from the start
    assert len(rows) == len(stages) * len(wf.depths)
    for r in rows[:: 37]:
        k, i = stages.index(r["stage"]), int(np.argmin(np.abs(wf.depths - float(r["depth [m]"]))))
        assert float(r["M [kNm/m]"]) == pytest.approx(wf.M[k, i], rel=1e-9, abs=1e-9)
        assert float(r["V [kN/m]"]) == pytest.approx(wf.V[k, i], rel=1e-9, abs=1e-9)
        assert float(r["ux [mm]"]) == pytest.approx(1e3 * wf.ux[k, i], rel=1e-9, abs=1e-12)
        s = float(r["M_std [kNm/m]"])
        assert float(r["M_high95 [kNm/m]"]) == pytest.approx(wf.M[k, i] + results.z * s, rel=1e-9, abs=1e-9)
    dug = {r["stage"]: float(r["excavation level [m]"]) for r in rows}
    assert [dug[s] for s in stages] == [4.0, 4.0, 9.0, 9.0, 14.0]
    sup = list(csv.DictReader(open(tmp_path / "supports.csv")))
    assert {(r["support"], r["stage"]) for r in sup} == {("P1", s) for s in stages[1:]} | {("P2", s) for s in stages[3:]}
    for r in sup:
        N, _ = sim.connector_force(v, r["support"], stages.index(r["stage"]))
        assert float(r["force per metre run [kN/m]"]) == pytest.approx(N, rel=1e-9, abs=1e-9)
        assert r["kind"] == "prop"
        if r["support"] == "P2":  # every 4 m: per prop
            assert float(r["force per support [kN]"]) == pytest.approx(4.0 * N, rel=1e-9, abs=1e-9)
        else:  # given per metre run: no force per prop
            assert r["force per support [kN]"] == "" and r["spacing [m]"] == ""
    assert float([r for r in sup if r["support"] == "P2" and r["stage"] == "level2"][0]["force_std [kN/m]"]) == 0.0


def test_support_stds_are_the_exact_propagation_and_agree_with_central_differences(model, results):
    loaded, sim, v = model
    stages = list(sim.stages)
    for name, s in results.supports.items():
        for k in range(stages.index(s.installed), len(stages)):
            F = _central(lambda u: sim.connector_force(u, name, k)[0], v, NAMES)
            assert s.std[k] == pytest.approx(std_of(F[None])[0], rel=1e-5, abs=1e-6)
    assert results.supports["P1"].std[-1] > 0


def test_wall_stds_agree_with_central_differences_of_another_step(model, results):
    loaded, sim, v = model
    w = results.walls["W"]
    F = _central(lambda u: sim.wall_forces(u)["W"].M[-1], v, NAMES, rel=1e-3)
    ref = std_of(F)
    big = np.abs(ref) > 1e-3 * np.abs(ref).max()
    assert np.allclose(w.M_std[-1][big], ref[big], rtol=2e-3)
    k, i = len(w.stages) - 1, int(np.nanargmax(np.abs(w.M[-1])))
    assert w.largest("M", k) == (pytest.approx(w.M[k, i]), pytest.approx(w.depths[i]), pytest.approx(w.M_std[k, i]))


def test_report_section_names_the_largest_moment_and_every_support(results):
    from geoback.reports.walls import report_section

    text = report_section(results)
    w = results.walls["W"]
    m, d, _ = w.largest("M", len(w.stages) - 1)
    assert "## Walls and supports" in text and f"{m:.3g} ± " in text and f"| {d:.1f} |" in text
    assert "| P2 (prop on 'W', every 4 m) | 7 | – | – | – |" in text and "kN per prop" in text


# ---------------------------------------------------------------------------- forecast kinds
def test_support_and_wall_forecasts_equal_direct_evaluation_with_central_difference_sensitivities(model):
    from geoback.worth.forecast import ForecastModel, _specs

    loaded, sim, v = model
    fm = ForecastModel(sim, _specs(loaded, list(sim.stages)))
    with fm.reading():
        q, A = fm(v, NAMES, sensitivities=True)
        rows = fm.layout(v)
        Acd = _central(lambda u: fm(u)[0], v, NAMES)
    last = len(sim.stages) - 1
    wf = sim.wall_forces(v)["W"]
    expected = np.concatenate([[4.0 * sim.connector_force(v, "P2", last)[0], sim.connector_force(v, "P1", last)[0]],
                               wf.M[last], wf.V[last]])
    assert np.allclose(q, expected, rtol=1e-12, atol=1e-9)
    scale = np.abs(A).max(axis=0)
    assert np.allclose(A, Acd, rtol=1e-4, atol=1e-5 * scale)
    units = {(r[0], r[3]): r[9] for r in rows}
    assert units == {("p2", "N"): "kN", ("p1", "N"): "kN/m", ("w", "M"): "kNm/m", ("w", "V"): "kN/m"}
    assert [r[6] for r in rows if r[0] == "w" and r[3] == "M"] == pytest.approx(list(wf.depths))


def test_a_load_cell_forecast_is_an_axial_force_in_kN(model):
    from geoback.reports.forecast_report import quantity_words
    from geoback.worth.forecast import ForecastModel, _specs

    data = case_data([{"name": "lc", "kind": "instrument", "instrument": "LC2", "stage": "dig3"}])
    data["instruments"].append({"name": "LC2", "kind": "load_cell", "support": "P2", "sigma": 10.0,
                                "readings": {"level2": [0.0]}})
    loaded = LoadedCase(case_from_data(data), None, {})
    sim = make_simulation(loaded, mesh=model[1].mesh)
    v = sim.quantities()
    fm = ForecastModel(sim, _specs(loaded, list(sim.stages)))
    with fm.reading():
        q, _ = fm(v)
        row = fm.layout(v)[0]
    assert q[0] == pytest.approx(4.0 * sim.connector_force(v, "P2", len(sim.stages) - 1)[0], rel=1e-9)
    assert row[9] == "kN"
    fake = type("F", (), {"quantity": ["N"], "kind": ["instrument"]})()
    assert quantity_words(fake, 0) == "axial force"


def test_bad_support_and_wall_forecasts_are_refused_located():
    e = _error(case_data([{"name": "f", "kind": "support", "support": "P9"}]))
    assert "forecasts[0].support" in e and "'P9'" in e and "P1, P2" in e
    e = _error(case_data([{"name": "f", "kind": "wall", "wall": "nowall"}]))
    assert "forecasts[0].wall" in e and "'nowall'" in e
    e = _error(case_data([{"name": "f", "kind": "support", "support": "P2", "stage": "dig2"}]))
    assert "forecasts[0].stage" in e and "installed ('level2')" in e and "'dig2'" in e
    e = _error(case_data([{"name": "f", "kind": "wall", "wall": "W", "quantities": ["N"]}]))
    assert "forecasts[0]" in e and "quantities" in e
    d = pit(props=False, size=1.0, far=8.0)
    d["construction"].pop("walls")
    d["instruments"] = [i for i in d["instruments"] if i["kind"] != "inclinometer"]
    d["forecasts"] = [{"name": "f", "kind": "wall", "wall": "W"}]
    e = _error(d)
    assert "forecasts[0].kind" in e and "retaining walls" in e


def test_a_bad_support_forecast_exits_2_through_the_cli(tmp_path):
    import yaml

    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(case_data([{"name": "f", "kind": "support", "support": "P9"}])))
    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "validate", str(path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2 and "forecasts[0].support" in out.stderr and "Traceback" not in out.stderr
    assert "bad.yaml" in out.stderr


# ---------------------------------------------------------------------------- figures and field.vtu
def _texts(fig):
    out = [fig.get_suptitle()] if hasattr(fig, "get_suptitle") else []
    for ax in fig.axes:
        out += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()]
        leg = ax.get_legend()
        if leg is not None:
            out += [t.get_text() for t in leg.get_texts()]
    for leg in fig.legends:
        out += [t.get_text() for t in leg.get_texts()]
    return out


def test_wall_and_support_figures_have_real_axes_and_stage_names(model, results, tmp_path):
    from geoback.reports.plots import save_figures
    from geoback.reports.plots.walls import supports_figure, walls_figure

    loaded, sim, v = model
    figs = {"walls": walls_figure(results), "supports": supports_figure(results)}
    texts = " | ".join(_texts(figs["walls"]))
    for want in ("deflection towards the excavation [mm]", "bending moment [kNm/m]", "shear force [kN/m]",
                 "depth below the ground surface [m]", "after 'dig3' (dug to 14 m)", "95 % band"):
        assert want in texts
    ax = figs["walls"].axes[0]
    lo, hi = ax.get_ylim()
    assert lo > hi and lo >= 24.0 and hi <= 0.0  # depth downwards, the whole wall
    levels = {round(line.get_ydata()[0], 6) for line in ax.lines if len(set(line.get_ydata())) == 1}
    assert {4.0, 9.0, 14.0, 1.5, 7.0} <= levels  # excavation levels and the props marked
    texts = " | ".join(_texts(figs["supports"]))
    assert "axial force per metre run of wall [kN/m]" in texts and "after 'level2'" in " ".join(
        t.get_text() for t in figs["supports"].axes[0].get_xticklabels())
    for t in ("wall_forces", "connector", "ux", "_"):
        assert t not in figs["walls"].get_suptitle() and t not in figs["supports"].get_suptitle()
    paths = save_figures(figs, tmp_path, ("png",))
    assert all(p.stat().st_size > 20_000 for p in paths)


def test_mesh_figure_draws_the_wall_in_its_own_colour_and_load_cells_apart(model):
    from matplotlib.colors import to_rgba

    from geoback.observation.instruments import case_blocks
    from geoback.reports.plots.mesh import WALL, mesh_figure

    data = case_data()
    data["instruments"].append({"name": "LC2", "kind": "load_cell", "support": "P2", "sigma": 10.0,
                                "readings": {"level2": [0.0]}})
    loaded = LoadedCase(case_from_data(data), None, {})
    _, sim, _ = model
    fig = mesh_figure(sim.mesh, loaded.case, case_blocks(loaded))
    texts = " | ".join(_texts(fig))
    assert "retaining wall 'W' (in place before construction)" in texts
    assert "LC2 (load cell on prop 'P2')" in texts and "linings' bands" not in texts
    faces = fig.axes[0].collections[0].get_facecolors()
    band = sim.mesh.band == list(sim.mesh.band_names).index("W")
    assert np.allclose(faces[band], to_rgba(WALL)) and not np.allclose(faces[~band][:5], to_rgba(WALL))
    assert fig.axes[1].get_title() == "Around the excavation"


def test_field_vtu_marks_the_wall_at_every_stage(model, tmp_path):
    import meshio

    from geoback.reports.report import write_field

    loaded, sim, v = model
    write_field(sim.field(v), tmp_path / "field.vtu", loaded.case)
    m = meshio.read(tmp_path / "field.vtu")
    band = sim.mesh.band == list(sim.mesh.band_names).index("W")
    wall = m.cell_data["wall"][0]
    assert np.array_equal(wall == 1, band) and band.any()
    for s in sim.stages:  # standing, as a band (1 + its index), from before the first stage
        assert np.all(m.cell_data[f"state[{s}]"][0][band] == 1 + list(sim.mesh.band_names).index("W"))


def test_anchors_tension_per_anchor_their_bands_and_the_summary(tmp_path):
    import json

    from geoback.reports.plots.walls import supports_figure
    from geoback.reports.walls import as_dict, write_walls
    from geoback.worth.walls import walls_and_supports

    data = pit(props=False, anchors=True, size=1.0, far=8.0, preload=80.0)
    loaded = LoadedCase(case_from_data(copy.deepcopy(data)), None, {})
    sim = make_simulation(loaded)
    v = sim.quantities()
    names = ["E[stiff]", "preload[P1]", "k[P2]"]
    ws = walls_and_supports(sim, loaded.case, v, names, std_of)
    stages = list(sim.stages)
    for name in ("P1", "P2"):
        s = ws.supports[name]
        assert s.kind == "anchor"
        for k in range(stages.index(s.installed), len(stages)):
            F = _central(lambda u: sim.connector_force(u, name, k)[0], v, names)
            assert s.std[k] == pytest.approx(std_of(F[None])[0], rel=1e-5, abs=1e-6)
    assert ws.supports["P1"].force[stages.index("level1")] == pytest.approx(80.0, rel=1e-9)  # locked off at 80
    write_walls(ws, tmp_path)
    rows = list(csv.DictReader(open(tmp_path / "supports.csv")))
    p2 = [r for r in rows if r["support"] == "P2"]
    assert {r["kind"] for r in rows} == {"anchor"} and all(r["spacing [m]"] == "2.5" for r in p2)
    for r in p2:
        assert float(r["force per support [kN]"]) == pytest.approx(2.5 * float(r["force per metre run [kN/m]"]))
    summary = json.loads(json.dumps(as_dict(ws)))  # JSON-ready
    last = summary["supports"]["P2"]["stages"][stages[-1]]
    assert last["force_per_support_kN"] == pytest.approx(2.5 * ws.supports["P2"].force[-1])
    assert summary["supports"]["P1"]["stages"]["dig1"]["force_kN_per_m"] is None  # not installed yet
    m = summary["walls"]["W"]["stages"][stages[-1]]
    assert (m["M_max_kNm_per_m"], m["M_max_depth_m"]) == pytest.approx(ws.walls["W"].largest("M", len(stages) - 1)[:2])
    texts = " | ".join(_texts(supports_figure(ws)))
    assert "anchor at 7 m on 'W' (tension +), every 2.5 m" in texts
