"""The shipped elastoplastic case through the commands: `geoback run` identifies E, K0, c' and phi' and
writes the plastic zone (plastic_zone.csv, a report section, summary.json, per-cell fields in
field.vtu); `geoback simulate` writes the plastic zone and its figure at the case's values."""
from __future__ import annotations

import csv
import json

import meshio
import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import load_case
from geoback.inference.identification import prepare
from geoback.commands.run import run_case
from geoback.inference.scale_estimates import chi2_ppf
from geoback.commands.simulate import simulate

PLASTIC = CASES / "plastic-tunnel.yaml"
TRUTH = {"E[marl]": 40000.0, "K0": 0.9, "c[marl]": 50.0, "phi[marl]": 30.0}  # cases/generate_plastic_tunnel.py


def rows(path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("plastic-run")
    return run_case(load_case(PLASTIC), out), out


def test_run_identifies_E_K0_c_and_phi(run):
    res, out = run
    assert res.status == "converged", res.fit.reason
    names = res.parameters.names
    assert names == list(TRUTH)
    e = res.fit.p - np.array([TRUTH[n] for n in names])
    d2 = float(e @ np.linalg.solve(res.reliability.covariance, e))
    assert d2 < chi2_ppf(0.99, len(names))  # the truth inside the 99 % confidence ellipsoid
    for n in names:
        assert abs(res[n].value - TRUTH[n]) < 3 * res[n].std, res[n]
    assert res["c[marl]"].std / res["c[marl]"].value < 0.15 and res["phi[marl]"].std < 3.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["forward_runs"] < 25 and summary["factorisations"] > summary["forward_runs"]


def test_plastic_zone_outputs(run):
    res, out = run
    table = rows(out / "plastic_zone.csv")
    whole = {r["stage"]: r for r in table if r["sector_deg"] == "all"}
    assert list(whole) == ["face-near", "face-past", "final"]
    assert int(whole["face-near"]["yielded_points"]) == 0  # half the stress released: still elastic
    R = 3.0
    near, final = float(whole["face-past"]["plastic_radius_m"]), float(whole["final"]["plastic_radius_m"])
    assert 1.05 * R < near < final and 1.3 * R < final < 1.8 * R
    sectors = [r for r in table if r["stage"] == "final" and r["sector_deg"] != "all"]
    assert len(sectors) == 12 and all(float(r["plastic_radius_m"]) > R for r in sectors)
    summary = json.loads((out / "summary.json").read_text())
    assert [z["stage"] for z in summary["plastic_zone"]] == ["face-near", "face-past", "final"]
    assert summary["plastic_zone"][-1]["max_radius_m"] == pytest.approx(final)
    report = (out / "report.md").read_text()
    assert "## Plastic zone" in report and "| final | 1 |" in report
    vtu = meshio.read(out / "field.vtu")
    for stage in ("face-near", "face-past", "final"):
        share = np.concatenate(vtu.cell_data[f"plastic[{stage}]"])
        strain = np.concatenate(vtu.cell_data[f"plastic_strain[{stage}]"])
        assert share.min() >= 0 and share.max() <= 1 and strain.min() >= 0
        assert (share.max() > 0) == (stage != "face-near")
        assert np.all(strain[share == 0] < 1e-12)  # no plastic strain where nothing yielded
    assert "displacement[face-past]" in vtu.point_data


def test_simulate_writes_the_plastic_zone(tmp_path):
    analysis = prepare(load_case(PLASTIC), with_readings=False)
    out = simulate(analysis, tmp_path)
    assert out["plastic_zone"].stages[-1].yielded_points > 0
    for name in ("plastic_zone.csv", "plastic_zone.png", "plastic_zone.svg", "predicted.csv", "field.vtu"):
        assert (tmp_path / name).stat().st_size > 0, name
    predicted = json.loads((tmp_path / "predicted.json").read_text())
    assert predicted["plastic_zone"][-1]["stage"] == "final"
    from geoback.reports.plots.plastic import plastic_zone_figure

    fig = plastic_zone_figure(out["plastic_zone"], name=analysis.case.name, case=analysis.case)
    assert fig._suptitle.get_text().split("\n")[0] == (f"{analysis.case.name}: plastic zone around the tunnel at the "
                                                        f"case's values")
    assert {"crown", "springline", "invert"} <= {t.get_text() for t in fig.axes[0].texts}
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend[0] == "after 'face-near' (release 0.5): the ground stays elastic"
    assert "reaches" in legend[-2] and "from the axis" in legend[-2] and legend[-1] == "tunnel wall (R = 3 m)"
